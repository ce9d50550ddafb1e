//! Training samples from an `ocm-tactile` dataset, and the split by set-up.

use ocm_tactile::dataset::Dataset;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::model::{Inputs, NpeConfig, Scales};
use crate::{NpeError, Result};

/// Finds the top node nearest to a point in x-y (within one bucket ring of 0.5 mm).
#[derive(Debug, Clone)]
pub struct NodeLocator {
    rest_m: Vec<[f64; 3]>,
    origin: [f64; 2],
    cell: f64,
    cols: usize,
    rows: usize,
    buckets: Vec<Vec<usize>>,
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
        let mut buckets = vec![Vec::new(); cols * rows];
        for (i, p) in rest_m.iter().enumerate() {
            let c = ((p[0] - lo[0]) / cell).floor() as usize;
            let r = ((p[1] - lo[1]) / cell).floor() as usize;
            buckets[r.min(rows - 1) * cols + c.min(cols - 1)].push(i);
        }
        NodeLocator {
            rest_m: rest_m.to_vec(),
            origin: lo,
            cell,
            cols,
            rows,
            buckets,
        }
    }

    /// The node nearest to (x, y) within about one bucket, if any.
    pub fn nearest(&self, x: f64, y: f64) -> Option<usize> {
        let c = ((x - self.origin[0]) / self.cell).floor();
        let r = ((y - self.origin[1]) / self.cell).floor();
        let mut best: Option<(f64, usize)> = None;
        for dr in -1..=1 {
            for dc in -1..=1 {
                let (rr, cc) = (r + f64::from(dr), c + f64::from(dc));
                if rr < 0.0 || cc < 0.0 || rr >= self.rows as f64 || cc >= self.cols as f64 {
                    continue;
                }
                for &i in &self.buckets[rr as usize * self.cols + cc as usize] {
                    let p = self.rest_m[i];
                    let d = (p[0] - x).powi(2) + (p[1] - y).powi(2);
                    if best.is_none_or(|(b, _)| d < b) {
                        best = Some((d, i));
                    }
                }
            }
        }
        best.map(|(_, i)| i)
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
        }
        x
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
        let mut seen: Vec<String> = p
            .setup_names
            .iter()
            .zip(&p.setup_unseen)
            .filter(|(_, u)| !**u)
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
            train: sorted(&seen[test + val..]),
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
