//! Training samples from an `ocm-tactile` dataset, and the split by set-up.

use ocm_tactile::dataset::Dataset;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::model::{Inputs, NpeConfig, Scales};
use crate::{NpeError, Result};

/// Reach of the gap input in x-y, m: a node with no contact point this near reads "far"
/// (distance 1 in the input's unit, height 0). The skirt the FEM drapes below the 30 um
/// threshold lies within one or two node spacings (about 0.4 mm each) of the contact.
pub const GAP_REACH_M: f64 = 1e-3;

/// Finds the top node nearest to a point in x-y (within one bucket ring of 0.5 mm).
#[derive(Debug, Clone)]
pub struct NodeLocator {
    rest_m: Vec<[f64; 3]>,
    origin: [f64; 2],
    cell: f64,
    cols: usize,
    rows: usize,
    /// Nodes of bucket `b`: `nodes[offsets[b]..offsets[b + 1]]`, in node order (one flat
    /// array: a call visits up to 25 buckets per point). Buckets are row-major, so the buckets
    /// of one row from column `c0` to `c1` are one range, `offsets[r * cols + c0]..offsets[r *
    /// cols + c1 + 1]`.
    offsets: Vec<usize>,
    nodes: Vec<usize>,
    /// x-y of `nodes[k]` at `k`: a search reads positions in the order it visits them.
    sorted_xy: Vec<[f64; 2]>,
}

impl NodeLocator {
    /// Buckets the nodes `rest_m` on a 0.5 mm grid.
    pub fn new(rest_m: &[[f64; 3]]) -> Self {
        let cell = 0.5e-3;
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for p in rest_m {
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        if rest_m.is_empty() {
            lo = [0.0; 2];
            hi = [0.0; 2];
        }
        let cols = ((hi[0] - lo[0]) / cell).floor() as usize + 1;
        let rows = ((hi[1] - lo[1]) / cell).floor() as usize + 1;
        let bucket = |p: &[f64; 3]| {
            let c = ((p[0] - lo[0]) / cell).floor() as usize;
            let r = ((p[1] - lo[1]) / cell).floor() as usize;
            r.min(rows - 1) * cols + c.min(cols - 1)
        };
        let mut offsets = vec![0usize; cols * rows + 1];
        for p in rest_m {
            offsets[bucket(p) + 1] += 1;
        }
        for b in 0..cols * rows {
            offsets[b + 1] += offsets[b];
        }
        let mut fill = offsets.clone();
        let mut nodes = vec![0usize; rest_m.len()];
        for (i, p) in rest_m.iter().enumerate() {
            let b = bucket(p);
            nodes[fill[b]] = i;
            fill[b] += 1;
        }
        let sorted_xy = nodes
            .iter()
            .map(|&i| [rest_m[i][0], rest_m[i][1]])
            .collect();
        NodeLocator {
            rest_m: rest_m.to_vec(),
            origin: lo,
            cell,
            cols,
            rows,
            offsets,
            nodes,
            sorted_xy,
        }
    }

    /// Positions in `nodes` (and `sorted_xy`) of the buckets of row `r` over `cols`.
    fn row_span(&self, r: usize, cols: &std::ops::Range<usize>) -> std::ops::Range<usize> {
        if cols.is_empty() {
            return 0..0;
        }
        self.offsets[r * self.cols + cols.start]..self.offsets[r * self.cols + cols.end]
    }

    /// Bucket rows and columns within one ring of the bucket holding (x, y), clipped to the
    /// grid (empty ranges when none is within it).
    fn ring(&self, x: f64, y: f64) -> (std::ops::Range<usize>, std::ops::Range<usize>) {
        let span = |v: f64, k: usize, n: usize| {
            let b = ((v - self.origin[k]) / self.cell).floor();
            // b in [-1, n] has a neighbour on the grid; NaN and far values give an empty range.
            if b >= -1.0 && b <= n as f64 {
                let b = b as i64;
                (b - 1).max(0) as usize..((b + 2) as usize).min(n)
            } else {
                0..0
            }
        };
        (span(y, 1, self.rows), span(x, 0, self.cols))
    }

    /// The node nearest to (x, y) within about one bucket, if any.
    pub fn nearest(&self, x: f64, y: f64) -> Option<usize> {
        let (rows, cols) = self.ring(x, y);
        // Visited in bucket order, and within a bucket in node order; the first of equally
        // near nodes wins.
        let mut best: Option<(f64, usize)> = None;
        for rr in rows {
            let span = self.row_span(rr, &cols);
            for (k, p) in span.clone().zip(&self.sorted_xy[span]) {
                let d = (p[0] - x).powi(2) + (p[1] - y).powi(2);
                if best.is_none_or(|(b, _)| d < b) {
                    best = Some((d, k));
                }
            }
        }
        best.map(|(_, k)| self.nodes[k])
    }

    /// Appends the scaled penetration of every node by `points` (the deepest point nearest to
    /// it; 0 for nodes no point is nearest to) to `out`.
    pub fn node_depth(&self, points_m: &[[f64; 3]], z_scale_m: f64, out: &mut Vec<f32>) {
        let start = out.len();
        out.resize(start + self.rest_m.len(), 0.0);
        for p in points_m {
            if let Some(i) = self.nearest(p[0], p[1]) {
                let d = ((self.rest_m[i][2] - p[2]).max(0.0) / z_scale_m) as f32;
                let v = &mut out[start + i];
                *v = v.max(d);
            }
        }
    }

    /// Appends the gap input of every node to `out`, two values per node: the x-y distance
    /// from the node to the nearest contact point over [`GAP_REACH_M`], and that point's
    /// height above the node's rest position over `z_scale_m` (negative where it presses the
    /// node down). Nodes with no point within the reach get (1, 0). Equally near points are
    /// decided by the lower one, so the order of `points_m` does not matter.
    ///
    /// `spacing_m` is the contact grid's spacing. When the points lie on such a grid (as
    /// `ContactGrid` makes them), only the points on the rim of the set (a grid neighbour
    /// missing) are searched over the whole reach; every node also looks up the (up to four)
    /// grid positions around it. That is exact: a node whose nearest point has all four grid
    /// neighbours lies within half a spacing of it in x and y (else the neighbour towards the
    /// node would be nearer), so that point is one of the four. Points off a grid are each
    /// searched over the whole reach.
    pub fn node_gap(
        &self,
        points_m: &[[f64; 3]],
        spacing_m: f64,
        z_scale_m: f64,
        out: &mut Vec<f32>,
    ) {
        let reach2 = GAP_REACH_M * GAP_REACH_M;
        let mut best = vec![(reach2, f64::INFINITY); self.rest_m.len()];
        let grid = PointGrid::new(points_m, spacing_m);
        let (rows, cols) = (self.rows as i64, self.cols as i64);
        let at = |v: f64, k: usize| ((v - self.origin[k]) / self.cell).floor() as i64;
        let offer = |b: &mut (f64, f64), d2: f64, z: f64| {
            if d2 < b.0 || (d2 == b.0 && z < b.1) {
                *b = (d2, z);
            }
        };
        for (k, p) in points_m.iter().enumerate() {
            if grid.as_ref().is_some_and(|g| g.interior[k]) {
                continue;
            }
            let h = GAP_REACH_M;
            let (c0, c1) = (at(p[0] - h, 0).max(0), at(p[0] + h, 0).min(cols - 1));
            let (r0, r1) = (at(p[1] - h, 1).max(0), at(p[1] + h, 1).min(rows - 1));
            if c0 > c1 {
                continue;
            }
            let reach_cols = c0 as usize..c1 as usize + 1;
            for rr in r0..=r1 {
                let span = self.row_span(rr as usize, &reach_cols);
                for (&i, q) in self.nodes[span.clone()].iter().zip(&self.sorted_xy[span]) {
                    let d2 = (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2);
                    offer(&mut best[i], d2, p[2]);
                }
            }
        }
        if let Some(g) = &grid {
            for (q, b) in self.rest_m.iter().zip(best.iter_mut()) {
                let fx = (q[0] - g.lo[0]) / g.spacing_m;
                let fy = (q[1] - g.lo[1]) / g.spacing_m;
                for x in [fx.floor(), fx.ceil()] {
                    for y in [fy.floor(), fy.ceil()] {
                        if let Some(k) = g.slot_at(x, y) {
                            let p = points_m[k];
                            let d2 = (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2);
                            offer(b, d2, p[2]);
                        }
                    }
                }
            }
        }
        out.reserve(2 * best.len());
        for (q, (d2, z)) in self.rest_m.iter().zip(best) {
            if z.is_finite() {
                out.push((d2.sqrt() / GAP_REACH_M) as f32);
                out.push(((z - q[2]) / z_scale_m) as f32);
            } else {
                out.extend([1.0, 0.0]);
            }
        }
    }
}

/// Contact points that lie on one grid: the lowest point of each grid position and which
/// points have all four grid neighbours.
struct PointGrid {
    lo: [f64; 2],
    spacing_m: f64,
    size: [usize; 2],
    /// Index of the lowest point at each grid position (`usize::MAX`: none).
    slot: Vec<usize>,
    /// Whether each point has points at +-spacing in x and in y.
    interior: Vec<bool>,
}

impl PointGrid {
    /// None when the points do not lie on one grid of `spacing_m` (or there are none).
    fn new(points_m: &[[f64; 3]], spacing_m: f64) -> Option<Self> {
        if points_m.is_empty() || !(spacing_m.is_finite() && spacing_m > 0.0) {
            return None;
        }
        let mut lo = [f64::INFINITY; 2];
        for p in points_m {
            lo = [lo[0].min(p[0]), lo[1].min(p[1])];
        }
        let mut ij = Vec::with_capacity(points_m.len());
        let mut size = [0usize; 2];
        for p in points_m {
            let mut idx = [0usize; 2];
            for k in 0..2 {
                let f = (p[k] - lo[k]) / spacing_m;
                let r = f.round();
                if (f - r).abs() > 1e-3 || r > 1e6 {
                    return None;
                }
                idx[k] = r as usize;
                size[k] = size[k].max(idx[k] + 1);
            }
            ij.push(idx);
        }
        if size[0].saturating_mul(size[1]) > 1 << 24 {
            return None;
        }
        let mut slot = vec![usize::MAX; size[0] * size[1]];
        for (k, &[i, j]) in ij.iter().enumerate() {
            let s = &mut slot[j * size[0] + i];
            if *s == usize::MAX || points_m[k][2] < points_m[*s][2] {
                *s = k;
            }
        }
        let on = |i: usize, j: usize| slot[j * size[0] + i] != usize::MAX;
        let interior = ij
            .iter()
            .map(|&[i, j]| {
                i > 0
                    && j > 0
                    && i + 1 < size[0]
                    && j + 1 < size[1]
                    && on(i - 1, j)
                    && on(i + 1, j)
                    && on(i, j - 1)
                    && on(i, j + 1)
            })
            .collect();
        Some(PointGrid {
            lo,
            spacing_m,
            size,
            slot,
            interior,
        })
    }

    /// The lowest point at grid position (x, y), if any.
    fn slot_at(&self, x: f64, y: f64) -> Option<usize> {
        if x < 0.0 || y < 0.0 || x >= self.size[0] as f64 || y >= self.size[1] as f64 {
            return None;
        }
        let k = self.slot[y as usize * self.size[0] + x as usize];
        (k != usize::MAX).then_some(k)
    }
}

/// Appends the contact gate of every node to `out`: 1 where the node's penetration
/// `node_depth` is positive or that of a node it shares an edge with, else 0. On the FEM data
/// set the one ring of neighbours carries the contact force the nearest-node lookup misses at
/// the patch's rim (at most 0.1 N, on the fine textures).
pub fn contact_gate(node_depth: &[f32], edges: &[[usize; 2]], out: &mut Vec<f32>) {
    let start = out.len();
    out.extend(node_depth.iter().map(|&d| if d > 0.0 { 1.0 } else { 0.0 }));
    for &[a, b] in edges {
        if node_depth[a] > 0.0 || node_depth[b] > 0.0 {
            out[start + a] = 1.0;
            out[start + b] = 1.0;
        }
    }
}

/// Whether two top faces, each as (rest positions in m, edges), are the same: the same edges
/// and every node within a nanometre (a surface stored in JSON keeps about that).
pub fn same_surface(a: (&[[f64; 3]], &[[usize; 2]]), b: (&[[f64; 3]], &[[usize; 2]])) -> bool {
    a.0.len() == b.0.len()
        && a.1 == b.1
        && a.0
            .iter()
            .zip(b.0)
            .all(|(p, q)| (0..3).all(|k| (p[k] - q[k]).abs() < 1e-9))
}

/// One sample, scaled for the network, with the physical values the metrics need.
#[derive(Debug, Clone)]
pub struct Sample {
    /// Index of its set-up in the dataset.
    pub setup: usize,
    /// Depth, m.
    pub depth_m: f64,
    /// Force of the gel on the indenter, N (its z component is the force input).
    pub force_n: [f64; 3],
    /// Contact points, sensor frame, m.
    pub points_m: Vec<[f64; 3]>,
    /// Scaled nodal (u, f), node-major, 6 per node.
    pub target: Vec<f32>,
}

/// Samples of a dataset with the top-face graph.
#[derive(Debug, Clone)]
pub struct Prepared {
    /// Set-up names, in dataset order.
    pub setup_names: Vec<String>,
    /// Whether each set-up is from the unseen set.
    pub setup_unseen: Vec<bool>,
    /// Every sample with at least one contact point.
    pub samples: Vec<Sample>,
    /// Samples left out because they have no contact point (the grid missed a tip).
    pub without_points: usize,
    /// Rest positions of the top nodes, m.
    pub rest_m: Vec<[f64; 3]>,
    /// Top-face edges.
    pub edges: Vec<[usize; 2]>,
    /// Contact grid spacing, m.
    pub spacing_m: f64,
    /// Nearest-node lookup on the top nodes.
    pub locator: NodeLocator,
}

impl Prepared {
    /// A copy of everything but the samples (set-ups, top face, grid), with none.
    pub fn without_samples(&self) -> Self {
        Self {
            setup_names: self.setup_names.clone(),
            setup_unseen: self.setup_unseen.clone(),
            samples: Vec::new(),
            without_points: 0,
            rest_m: self.rest_m.clone(),
            edges: self.edges.clone(),
            spacing_m: self.spacing_m,
            locator: self.locator.clone(),
        }
    }

    /// Scales every sample's targets with `scales`.
    pub fn from_dataset(ds: &Dataset, scales: &Scales) -> Self {
        let mut samples = Vec::new();
        let mut without_points = 0;
        for (si, s) in ds.setups.iter().enumerate() {
            for k in 0..s.depth_m.len() {
                if s.points_m[k].is_empty() {
                    without_points += 1;
                    continue;
                }
                let mut target = Vec::with_capacity(6 * s.displacement_m[k].len());
                for (u, f) in s.displacement_m[k].iter().zip(&s.nodal_force_n[k]) {
                    target.extend(u.map(|v| (v / scales.displacement_m) as f32));
                    target.extend(f.map(|v| (v / scales.nodal_force_n) as f32));
                }
                samples.push(Sample {
                    setup: si,
                    depth_m: s.depth_m[k],
                    force_n: s.force_n[k],
                    points_m: s.points_m[k].clone(),
                    target,
                });
            }
        }
        Prepared {
            setup_names: ds.setups.iter().map(|s| s.name.clone()).collect(),
            setup_unseen: ds.setups.iter().map(|s| s.unseen).collect(),
            samples,
            without_points,
            rest_m: ds.top_rest_m.clone(),
            edges: ds.top_edges.clone(),
            spacing_m: ds.manifest.options.grid_spacing_m,
            locator: NodeLocator::new(&ds.top_rest_m),
        }
    }

    /// Centre of the top face (x, y) and its highest point (z), m.
    pub fn top_center(rest_m: &[[f64; 3]]) -> [f64; 3] {
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        let mut z: f64 = f64::NEG_INFINITY;
        for p in rest_m {
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
            z = z.max(p[2]);
        }
        [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), z]
    }

    /// The scaled inputs of samples `idx`.
    pub fn inputs(&self, cfg: &NpeConfig, idx: &[usize]) -> Inputs {
        let mut x = Inputs::default();
        for &i in idx {
            let s = &self.samples[i];
            x.counts.push(s.points_m.len());
            for p in &s.points_m {
                x.points.extend(cfg.scales.point(p));
            }
            x.scalars.push((s.force_n[2] / cfg.scales.force_n) as f32);
            x.scalars.push((s.depth_m / cfg.scales.depth_m) as f32);
            let at = x.node_depth.len();
            self.locator
                .node_depth(&s.points_m, cfg.scales.z_m, &mut x.node_depth);
            if cfg.contact_prior {
                contact_gate(&x.node_depth[at..], &self.edges, &mut x.node_gate);
            }
            if cfg.node_gap {
                self.locator.node_gap(
                    &s.points_m,
                    cfg.grid_spacing_m(),
                    cfg.scales.z_m,
                    &mut x.node_gap,
                );
            }
        }
        x
    }

    /// Appends the set-ups and samples of `other`, a data set of the same top face (rest
    /// positions, edges and contact grid), e.g. extra placements for training only.
    pub fn append(&mut self, other: Prepared) -> Result<()> {
        if !same_surface((&other.rest_m, &other.edges), (&self.rest_m, &self.edges)) {
            return Err(NpeError::Data(format!(
                "the data set to append has another top surface ({} nodes, {} edges; this one \
                 {} nodes, {} edges)",
                other.rest_m.len(),
                other.edges.len(),
                self.rest_m.len(),
                self.edges.len()
            )));
        }
        if (other.spacing_m - self.spacing_m).abs() > 1e-12 {
            return Err(NpeError::Data(format!(
                "the data set to append has contact grid spacing {} m, this one {} m",
                other.spacing_m, self.spacing_m
            )));
        }
        if let Some(name) = other
            .setup_names
            .iter()
            .find(|n| self.setup_names.contains(n))
        {
            return Err(NpeError::Data(format!(
                "set-up '{name}' is in both data sets"
            )));
        }
        let offset = self.setup_names.len();
        self.setup_names.extend(other.setup_names);
        self.setup_unseen.extend(other.setup_unseen);
        self.without_points += other.without_points;
        self.samples.extend(other.samples.into_iter().map(|mut s| {
            s.setup += offset;
            s
        }));
        Ok(())
    }

    /// Sample indices of the named set-ups.
    pub fn samples_of(&self, names: &[String]) -> Vec<usize> {
        (0..self.samples.len())
            .filter(|&i| names.contains(&self.setup_names[self.samples[i].setup]))
            .collect()
    }
}

/// Set-ups for training, validation (early stopping), the held-out seen test and the unseen
/// indenters.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SetupSplit {
    /// Set-ups the optimiser sees.
    pub train: Vec<String>,
    /// Set-ups that pick the best epoch.
    pub val: Vec<String>,
    /// Held-out seen set-ups, scored only.
    pub test: Vec<String>,
    /// Unseen indenters, scored only.
    pub unseen: Vec<String>,
}

impl SetupSplit {
    /// A seeded split of the seen set-ups: `test` and `val` of them held out.
    pub fn new(p: &Prepared, test: usize, val: usize, seed: u64) -> Result<Self> {
        Self::with_train_only(p, test, val, seed, &[])
    }

    /// [`SetupSplit::new`] over the seen set-ups other than `train_only`, which all go to
    /// training: extra set-ups leave the held-out ones as they were without them.
    pub fn with_train_only(
        p: &Prepared,
        test: usize,
        val: usize,
        seed: u64,
        train_only: &[String],
    ) -> Result<Self> {
        for name in train_only {
            match p.setup_names.iter().position(|n| n == name) {
                None => {
                    return Err(NpeError::Input(format!(
                        "training-only set-up '{name}' is not in the data"
                    )));
                }
                Some(i) if p.setup_unseen[i] => {
                    return Err(NpeError::Input(format!(
                        "set-up '{name}' is of an unseen indenter and cannot be trained on"
                    )));
                }
                Some(_) => {}
            }
        }
        let mut seen: Vec<String> = p
            .setup_names
            .iter()
            .zip(&p.setup_unseen)
            .filter(|(n, u)| !**u && !train_only.contains(n))
            .map(|(n, _)| n.clone())
            .collect();
        seen.sort();
        if seen.len() < test + val + 1 {
            return Err(NpeError::Data(format!(
                "{} seen set-ups cannot be split into {test} test, {val} validation and training",
                seen.len()
            )));
        }
        seen.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
        let sorted = |v: &[String]| {
            let mut v = v.to_vec();
            v.sort();
            v
        };
        Ok(SetupSplit {
            test: sorted(&seen[..test]),
            val: sorted(&seen[test..test + val]),
            train: {
                let mut t = sorted(&[&seen[test + val..], train_only].concat());
                t.dedup();
                t
            },
            unseen: sorted(
                &p.setup_names
                    .iter()
                    .zip(&p.setup_unseen)
                    .filter(|(_, u)| **u)
                    .map(|(n, _)| n.clone())
                    .collect::<Vec<_>>(),
            ),
        })
    }
}
