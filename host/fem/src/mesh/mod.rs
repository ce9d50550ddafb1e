//! Tetrahedral meshes and their file formats.

pub mod generate;
pub mod stl;
pub mod surface;
pub mod vtk;

use std::collections::BTreeMap;

/// A mesh of linear tetrahedra and triangles sharing one point list.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Mesh {
    /// Point coordinates, in the file's units.
    pub points: Vec<[f64; 3]>,
    /// Linear tetrahedra (VTK type 10), point indices.
    pub tets: Vec<[usize; 4]>,
    /// Triangles (VTK type 5), point indices.
    pub triangles: Vec<[usize; 3]>,
    /// Cells of other types that were skipped: VTK cell type -> count.
    pub skipped: BTreeMap<u8, usize>,
}

impl Mesh {
    /// Scales all coordinates (e.g. 1e-3 to go from millimetres to metres).
    pub fn scale(&mut self, factor: f64) {
        for p in &mut self.points {
            for c in p.iter_mut() {
                *c *= factor;
            }
        }
    }

    /// Axis-aligned bounding box (min, max); zeros for an empty mesh.
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        if self.points.is_empty() {
            return ([0.0; 3], [0.0; 3]);
        }
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in &self.points {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        (lo, hi)
    }

    /// Signed volume of tetrahedron `t` (positive when a-b-c is counter-clockwise seen from d's opposite side).
    pub fn tet_volume(&self, t: usize) -> f64 {
        let [a, b, c, d] = self.tets[t];
        let p = |i: usize| nalgebra::Vector3::from(self.points[i]);
        let (pa, pb, pc, pd) = (p(a), p(b), p(c), p(d));
        (pb - pa).cross(&(pc - pa)).dot(&(pd - pa)) / 6.0
    }

    /// Reorders tets with negative signed volume so that all are positively oriented.
    pub fn orient_tets(&mut self) -> usize {
        let mut flipped = 0;
        for t in 0..self.tets.len() {
            if self.tet_volume(t) < 0.0 {
                self.tets[t].swap(2, 3);
                flipped += 1;
            }
        }
        flipped
    }

    /// Drops points referenced by no tet (e.g. Gmsh's geometry vertices), remapping indices.
    /// Triangles that reference a dropped point are dropped too. Returns the old->new map.
    pub fn remove_unused_points(&mut self) -> Vec<Option<usize>> {
        let mut used = vec![false; self.points.len()];
        for t in &self.tets {
            for &i in t {
                used[i] = true;
            }
        }
        let mut map = vec![None; self.points.len()];
        let mut pts = Vec::new();
        for (i, p) in self.points.iter().enumerate() {
            if used[i] {
                map[i] = Some(pts.len());
                pts.push(*p);
            }
        }
        self.points = pts;
        for t in &mut self.tets {
            for i in t.iter_mut() {
                *i = map[*i].unwrap_or(0);
            }
        }
        self.triangles = self
            .triangles
            .iter()
            .filter_map(|tr| Some([map[tr[0]]?, map[tr[1]]?, map[tr[2]]?]))
            .collect();
        map
    }

    /// Checks that every index is in range and every coordinate finite.
    pub fn validate(&self) -> crate::Result<()> {
        let n = self.points.len();
        if let Some(i) = self
            .points
            .iter()
            .position(|p| p.iter().any(|c| !c.is_finite()))
        {
            return Err(crate::FemError::Model(format!(
                "point {i} has a non-finite coordinate"
            )));
        }
        for (k, t) in self.tets.iter().enumerate() {
            if let Some(&i) = t.iter().find(|&&i| i >= n) {
                return Err(crate::FemError::Model(format!(
                    "tet {k} references point {i}, but there are {n} points"
                )));
            }
        }
        for (k, t) in self.triangles.iter().enumerate() {
            if let Some(&i) = t.iter().find(|&&i| i >= n) {
                return Err(crate::FemError::Model(format!(
                    "triangle {k} references point {i}, but there are {n} points"
                )));
            }
        }
        Ok(())
    }
}
